//! Turntable firmware for a Raspberry Pi Pico (RP2040).
//!
//! The shared protocol logic ([`turntable_proto::Device`]) answers on UART0 (GP0 TX, GP1 RX,
//! 115200 8N1) and on USB-CDC at once. It drives a STEP/DIR/EN stepper driver (A4988, DRV8825,
//! TMC2209 in STEP/DIR mode): STEP on GP2, DIR on GP3, EN on GP4 (active low). EN is released
//! while an alarm is active, so an emergency stop frees the motor.
#![no_std]
#![no_main]

use core::fmt::Write as _;
use embassy_executor::Spawner;
use embassy_rp::bind_interrupts;
use embassy_rp::gpio::{Level, Output};
use embassy_rp::peripherals::{UART0, USB};
use embassy_rp::uart::{BufferedInterruptHandler, BufferedUart, BufferedUartRx, BufferedUartTx, Config as UartConfig};
use embassy_rp::usb::{Driver, InterruptHandler as UsbInterruptHandler};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::channel::Channel;
use embassy_time::{Instant, Timer};
use embassy_usb::class::cdc_acm::{CdcAcmClass, Receiver, Sender, State as CdcState};
use embassy_usb::{Builder, Config as UsbConfig, UsbDevice};
use embedded_io_async::{Read, Write};
use heapless::String;
use panic_halt as _;
use static_cell::StaticCell;
use turntable_proto::{Config, Device, Sink, State};

bind_interrupts!(struct Irqs {
    UART0_IRQ => BufferedInterruptHandler<UART0>;
    USBCTRL_IRQ => UsbInterruptHandler<USB>;
});

/// One reply line.
type Line = String<128>;

/// The device, shared by the two links and the stepper task.
static DEVICE: Mutex<CriticalSectionRawMutex, core::cell::RefCell<Option<Device>>> =
    Mutex::new(core::cell::RefCell::new(None));
/// Replies fan out to both links; a link that is not read drops its oldest-pending lines.
static TO_UART: Channel<CriticalSectionRawMutex, Line, 32> = Channel::new();
static TO_USB: Channel<CriticalSectionRawMutex, Line, 32> = Channel::new();

struct Fanout;

impl Sink for Fanout {
    fn send(&mut self, line: &str) {
        let mut l = Line::new();
        let _ = writeln!(l, "{line}");
        // try_send: a full queue (nobody listening on that link) must never block the motor.
        let _ = TO_UART.try_send(l.clone());
        let _ = TO_USB.try_send(l);
    }
}

fn now_us() -> u64 {
    Instant::now().as_micros()
}

fn with_device<R>(f: impl FnOnce(&mut Device) -> R) -> Option<R> {
    DEVICE.lock(|d| d.borrow_mut().as_mut().map(f))
}

fn feed(bytes: &[u8]) {
    with_device(|d| {
        for &b in bytes {
            d.feed(b, now_us(), &mut Fanout);
        }
    });
}

/// Follows the commanded position with STEP pulses and polls the device every 100 µs.
#[embassy_executor::task]
async fn stepper_task(mut step: Output<'static>, mut dir: Output<'static>, mut en: Output<'static>) {
    let mut at: i64 = 0;
    loop {
        let (target, alarm) = with_device(|d| {
            let t = now_us();
            d.poll(t, &mut Fanout);
            (d.physical_position(t), d.state() == State::Alarm)
        })
        .unwrap_or((at, false));
        if alarm {
            en.set_high()
        } else {
            en.set_low()
        }
        while at != target && !alarm {
            if target > at {
                dir.set_high()
            } else {
                dir.set_low()
            }
            // A4988/TMC2209 need ≥1 µs high and low; 2 µs each keeps up to 250 k steps/s.
            step.set_high();
            Timer::after_micros(2).await;
            step.set_low();
            Timer::after_micros(2).await;
            at += if target > at { 1 } else { -1 };
        }
        if alarm {
            at = target; // e-stop halts the commanded position where the motor was released
        }
        Timer::after_micros(100).await;
    }
}

#[embassy_executor::task]
async fn uart_rx_task(mut rx: BufferedUartRx) {
    let mut buf = [0u8; 64];
    loop {
        if let Ok(n) = rx.read(&mut buf).await {
            feed(&buf[..n]);
        }
    }
}

#[embassy_executor::task]
async fn uart_tx_task(mut tx: BufferedUartTx) {
    loop {
        let line = TO_UART.receive().await;
        let _ = tx.write_all(line.as_bytes()).await;
    }
}

type UsbDrv = Driver<'static, USB>;

#[embassy_executor::task]
async fn usb_task(mut dev: UsbDevice<'static, UsbDrv>) -> ! {
    dev.run().await
}

#[embassy_executor::task]
async fn cdc_rx_task(mut rx: Receiver<'static, UsbDrv>) {
    let mut buf = [0u8; 64];
    loop {
        rx.wait_connection().await;
        while let Ok(n) = rx.read_packet(&mut buf).await {
            feed(&buf[..n]);
        }
    }
}

#[embassy_executor::task]
async fn cdc_tx_task(mut tx: Sender<'static, UsbDrv>) {
    loop {
        tx.wait_connection().await;
        loop {
            let line = TO_USB.receive().await;
            // Packets are at most 64 bytes; a line is sent in as many as it needs.
            let mut ok = true;
            for chunk in line.as_bytes().chunks(64) {
                ok &= tx.write_packet(chunk).await.is_ok();
            }
            if !ok {
                break;
            }
        }
    }
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_rp::init(Default::default());
    DEVICE.lock(|d| {
        let mut dev = Device::new(Config { fw_version: "0.2.0-rp2040", ..Config::default() }, now_us());
        dev.reset(now_us(), &mut Fanout);
        *d.borrow_mut() = Some(dev);
    });
    let step = Output::new(p.PIN_2, Level::Low);
    let dir = Output::new(p.PIN_3, Level::Low);
    let en = Output::new(p.PIN_4, Level::High);
    spawner.spawn(stepper_task(step, dir, en).unwrap());

    static TXB: StaticCell<[u8; 256]> = StaticCell::new();
    static RXB: StaticCell<[u8; 256]> = StaticCell::new();
    let mut ucfg = UartConfig::default();
    ucfg.baudrate = 115_200;
    let uart = BufferedUart::new(p.UART0, p.PIN_0, p.PIN_1, Irqs, TXB.init([0; 256]), RXB.init([0; 256]), ucfg);
    let (tx, rx) = uart.split();
    spawner.spawn(uart_rx_task(rx).unwrap());
    spawner.spawn(uart_tx_task(tx).unwrap());

    let driver = Driver::new(p.USB, Irqs);
    let mut config = UsbConfig::new(0x16c0, 0x27dd);
    config.manufacturer = Some("pav");
    config.product = Some("pav turntable");
    config.serial_number = Some("0001");
    config.max_power = 100;
    config.max_packet_size_0 = 64;
    static CFG_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static BOS_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static CTRL: StaticCell<[u8; 64]> = StaticCell::new();
    static STATE: StaticCell<CdcState> = StaticCell::new();
    let mut builder =
        Builder::new(driver, config, CFG_DESC.init([0; 256]), BOS_DESC.init([0; 256]), &mut [], CTRL.init([0; 64]));
    let class = CdcAcmClass::new(&mut builder, STATE.init(CdcState::new()), 64);
    let usb = builder.build();
    let (tx, rx) = class.split();
    spawner.spawn(usb_task(usb).unwrap());
    spawner.spawn(cdc_rx_task(rx).unwrap());
    spawner.spawn(cdc_tx_task(tx).unwrap());
}
